"""``python -m landfall_train``: render, train, calibrate and export LandNet-S (landfall_train.train)."""

from landfall_train.train import main

raise SystemExit(main())
