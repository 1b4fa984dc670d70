"""Evaluation tools: metrics against ground truth."""
