"""A real headless Chromium (Debian's `chromium`, driven by selenium through
`chromium-driver`) for the tests of linkevo's pages and of the MLflow UI."""

from __future__ import annotations

import os
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

CHROMIUM = Path("/usr/bin/chromium")
CHROMEDRIVER = Path("/usr/bin/chromedriver")


@contextmanager
def chromium(profile: Path | None = None, size: str = "1400,1000") -> Iterator[object]:
    """Yields a headless Chromium webdriver; `profile` makes it start from that (empty)
    user-data folder, as a browser that never saw the page would."""
    for program, package in ((CHROMIUM, "chromium"), (CHROMEDRIVER, "chromium-driver")):
        if not os.access(program, os.X_OK):
            raise RuntimeError(
                f"this test drives a real browser and {program} is missing; install it with: "
                f"sudo apt-get install -y {package} (tests/system-packages.sh does, as root)"
            )
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    arguments = ["--headless=new", "--no-sandbox", "--disable-gpu", f"--window-size={size}"]
    if profile is not None:
        arguments.append(f"--user-data-dir={profile}")
    for argument in arguments:
        options.add_argument(argument)
    driver = webdriver.Chrome(options=options, service=Service(str(CHROMEDRIVER)))
    try:
        yield driver
    finally:
        driver.quit()
