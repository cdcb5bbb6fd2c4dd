"""Segue's engines: each builds a database from a motion library and answers synthesis requests."""
