#!/usr/bin/env python3
"""Send an alarm to the Landfall companion: ``trigger_alarm.py --reason TEXT --criticality high``."""

import sys

from companion.alarm_cli import main

if __name__ == "__main__":
    sys.exit(main())
