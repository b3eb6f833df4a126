import sys

from simbridge.cli import main

sys.exit(main())
