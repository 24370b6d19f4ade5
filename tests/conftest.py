import os

from hypothesis import settings

os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")

# The suite gives the same verdict on every run: property tests draw a fixed set of examples. To hunt
# for new failures with fresh random draws: HYPOTHESIS_PROFILE=explore python -m pytest tests/test_cli_property.py
settings.register_profile("suite", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "suite"))
