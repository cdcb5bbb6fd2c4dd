"""The motion-graph engine (Arikan & Forsyth 2002): hierarchical graph + randomized anytime search."""
