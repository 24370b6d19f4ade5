"""`python -m zodrive`: the `zodrive` command line (`zodrive.cli.main`), with its exit status."""

import sys

from zodrive.cli import main

sys.exit(main())
