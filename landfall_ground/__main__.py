import sys

from landfall_ground.cli import main

sys.exit(main())
