"""Control by example (Hsu, Gentry & Popović 2004): a target motion driven by a control motion,
interpreted as a sequence of stretched, rigidly aligned database segments by dynamic programming."""
