"""Baseline drivers: constant actions, observation-reading rules and simulator-reading planners,
the floors and teachers learned policies are measured against (`baseline:NAME`)."""
