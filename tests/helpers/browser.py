"""A real headless Chromium (Debian's `chromium`, driven by selenium through
`chromium-driver`) for the tests of linkevo's pages and of the MLflow UI."""

from __future__ import annotations

import os
import time
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


def open_explorer(browser, path: Path) -> None:
    """Opens an explorer page from disk and waits until it has inflated its data."""
    browser.get(path.resolve().as_uri())
    deadline = time.monotonic() + 20
    while not browser.execute_script("return !!(window.explorer && window.explorer.ready)"):
        assert time.monotonic() < deadline, "the explorer page did not load its data"
        time.sleep(0.05)


def point_at(browser, cell: int, click: bool = False) -> None:
    """Moves the real mouse over an explorer map's cell (and clicks it)."""
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    where = browser.execute_script("return window.explorer.cellCenter(arguments[0])", cell)
    canvas = browser.find_element(By.ID, "map")
    size = canvas.size  # selenium's offsets count from the element's centre
    chain = ActionChains(browser).move_to_element_with_offset(
        canvas, round(where["x"] - size["width"] / 2), round(where["y"] - size["height"] / 2)
    )
    (chain.click() if click else chain).perform()
