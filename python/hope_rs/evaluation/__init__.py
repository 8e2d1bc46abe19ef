"""Scoring maps against ground truth, benchmark runs, the demo and pictures of maps."""
