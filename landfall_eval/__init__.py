"""The evaluation harness: ground truth from simbridge, metrics, and companion-bench.

It grades with simbridge's ground truth, never with the companion's beliefs.
"""
