"""`python -m orchestrator ...` is `immerse ...` (orchestrator/cli.py)."""
import sys

from orchestrator.cli import main

sys.exit(main())
