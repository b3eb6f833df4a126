"""Training tools for the onboard image judgement: labelled patches rendered by simbridge,
image-space randomisation, LandNet-S and its training, export and calibration (``python -m
landfall_train``; ``make model``). A tool package above both ``companion`` and ``simbridge``: nothing that
flies imports it, and torch is needed only here (the ``train`` extra)."""

from landfall_train.labels import CLASSES, label_map

__all__ = ["CLASSES", "label_map"]
