"""Synthetic generators and real-data loaders."""
