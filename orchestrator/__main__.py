"""Runs the `linkevo` CLI as `python -m orchestrator`."""

import sys

from orchestrator.cli import main

sys.exit(main())
