"""The evaluation harness: ground truth from simbridge, metrics, and (issue 7) companion-bench.

It grades with simbridge's ground truth, never with the companion's beliefs.
"""
