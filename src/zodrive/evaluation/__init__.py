"""Evaluation: episodes of a policy (attacked or clean) and what is measured on them, with
confidence intervals, reports, videos and per-state certificates."""
