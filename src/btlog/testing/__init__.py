"""Testing support: the pytest plugin and helpers for regression tests on stored runs."""
