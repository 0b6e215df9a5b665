"""Adapters to other ecosystems (optional extras; each module imports its own dependencies)."""
