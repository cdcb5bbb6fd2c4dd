"""Segue's job runtime: the store, job execution, and the embedded and Redis job backends."""
