"""Simulated domains from the paper: the kitting task and the Taxi domain.

``make_domain(name, seed)`` returns the domain a run uses; ``scripted`` (the default)
runs any tree from its outcomes alone.
"""

from __future__ import annotations

from btlog.domains.base import Domain


def domain_names() -> list[str]:
    """The names accepted by ``--domain``."""
    return ["scripted", "kitting", "taxi"]


def make_domain(name: str, seed: int = 0) -> Domain:
    """A fresh domain instance for one run (ValueError for an unknown name)."""
    if name == "kitting":
        from btlog.domains.kitting import KittingDomain

        return KittingDomain(seed)
    if name == "taxi":
        from btlog.domains.taxi import TaxiDomain

        return TaxiDomain(seed)
    if name == "scripted":
        return Domain(seed)
    raise ValueError(f"unknown domain {name!r} (choose from {', '.join(domain_names())})")
