"""Reasoning tiers: which candidate is safest, and is this site still safe for the next step down."""

from companion.reasoning.onboard import Decision, OnboardReasoner, Ranking, Reasoner

__all__ = ["Decision", "OnboardReasoner", "Ranking", "Reasoner"]
