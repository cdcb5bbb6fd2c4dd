"""Segue's front door: the command-line interface (and, with the service issue, the HTTP API)."""
