"""zodrive: black-box observation attacks on deep-RL driving policies, and defenses."""

__version__ = "0.1.0"
