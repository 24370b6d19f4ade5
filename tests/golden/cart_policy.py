"""A CartPole policy that always pushes left (a user's FILE.py:NAME for tests)."""
import numpy as np
def make():
    return lambda obs: np.tile(np.array([[1.0, 0.0]], np.float32), (np.asarray(obs).reshape(-1, 4).shape[0], 1))
