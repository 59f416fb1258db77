"""Test settings: property tests are derandomized by default, so that `make test` (and CI) is
reproducible; set HYPOTHESIS_PROFILE=explore to search with fresh random examples."""

import os

from hypothesis import settings

settings.register_profile("default", derandomize=True)
settings.register_profile("explore", derandomize=False, max_examples=500)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "default"))
