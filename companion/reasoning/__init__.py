"""Reasoning tiers: which candidate is safest, and is this site still safe for the next step down.

- ``base``: the requests, answers and typed failures every tier shares;
- ``cascade``: the deadline-driven tier order and the confirmation arbitration; ``tiers`` builds it from
  the configuration;
- ``lvlm``: the OpenAI-compatible vision-language client; ``prompts`` and ``parsing``: what we ask
  models and how we read their answers;
- ``onboard``: the onboard tier, with its parameters in ``onboard_params``; it judges images with
  ``landnet`` (the learned judge's runtime: LandNet-S or LandNet-E and its whole-image read, weights in
  ``models/``) through ``net_judge``, or with the image cues (``image_cues``, the pipeline, with
  ``cue_params``, ``cue_surface``, ``cue_objects`` and ``cue_verdict``).
"""

from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner, ReasonerError

__all__ = ["ConfirmRequest", "Decision", "RankRequest", "Ranking", "Reasoner", "ReasonerError"]
