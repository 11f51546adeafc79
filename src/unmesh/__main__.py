import sys

from unmesh.cli import main

sys.exit(main())
