"""The default tick gap of the importers that infer ticks (``btlog.sources.builder``, rule
3), in a module of its own so the command line can show it without importing them."""

#: A gap between two transitions longer than this starts a new tick (rule 3).
DEFAULT_TICK_GAP_NS = 1_000_000
