"""Root pytest configuration: keep modules with side effects out of doctest collection."""

collect_ignore = ["src/transync/__main__.py"]
