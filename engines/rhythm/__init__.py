"""Rhythmic-motion synthesis (Kim, Park & Shin 2003): see :mod:`engines.rhythm.engine`."""
