"""Landfall companion service."""
