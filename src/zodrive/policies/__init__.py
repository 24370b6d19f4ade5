"""Policies: whatever a user passes, resolved once into a `Policy` (see `policy.py`)."""
