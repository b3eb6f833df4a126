"""Reasoning tiers: which candidate is safest, and is this site still safe for the next step down.

``base`` holds the requests, answers and typed failures every tier shares; ``onboard`` the deterministic
scorer; ``lvlm`` the OpenAI-compatible vision-language client; ``cascade`` the deadline-driven tier order
and the confirmation arbitration; ``prompts`` and ``parsing`` what we ask models and how we read them.
"""

from companion.reasoning.base import ConfirmRequest, Decision, Ranking, RankRequest, Reasoner, ReasonerError

__all__ = ["ConfirmRequest", "Decision", "RankRequest", "Ranking", "Reasoner", "ReasonerError"]
