"""Test configuration: hypothesis runs a fixed, derandomized set of examples."""

from hypothesis import settings

# No unseeded randomness anywhere, tests included: the same examples every run.
settings.register_profile("warpcli", derandomize=True, deadline=None, max_examples=40)
settings.load_profile("warpcli")
