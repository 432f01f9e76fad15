"""Adapters for other multi-agent libraries, imported only where they are installed."""
