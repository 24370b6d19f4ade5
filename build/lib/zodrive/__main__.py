import sys

from zodrive.cli import main

sys.exit(main())
