"""Simulated domains from the paper: the kitting task and the Taxi domain."""
