"""Motion synthesis from annotations (Arikan, Forsyth & O'Brien 2003): SVM label propagation and a
coarse-to-fine dynamic-programming search over blocks of database frames."""
