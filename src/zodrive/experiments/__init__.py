"""Experiments: grids of evaluation cells (compare, bench, reproduce) and the tables, figures,
cards and leaderboards made from their results."""
