"""Runs the `linkevo` CLI as `python -m linkevo.orchestrator`."""

import sys

from linkevo.orchestrator.cli import main

sys.exit(main())
