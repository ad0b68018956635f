"""Applications on top of the library: the command line, the reproduction of the paper, the
figures, the benchmark, tuning and the pedestrian evaluation."""
