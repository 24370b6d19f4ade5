import os

import torch
from hypothesis import settings

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")
# The suite runs on two worker processes (`-n 2` in pyproject.toml). Its networks are small, so one torch
# thread per process is fastest; with torch's default of one thread per core the two workers fight for
# the cores and the suite takes longer than in one process. Subprocesses that tests start inherit it.
os.environ["OMP_NUM_THREADS"] = "1"
torch.set_num_threads(1)

# The suite gives the same verdict on every run: property tests draw a fixed set of examples. To hunt
# for new failures with fresh random draws: HYPOTHESIS_PROFILE=explore python -m pytest tests/test_cli_property.py
settings.register_profile("suite", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))
