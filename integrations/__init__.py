"""Clients of Segue that live inside other programs, over the HTTP API only (never importing Segue)."""
