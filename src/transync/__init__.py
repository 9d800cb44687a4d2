"""transync: transformation synchronization for graph matching and multi-view geometry."""

__version__ = "0.1.0"
