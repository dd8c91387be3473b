"""What a command does end to end: one run, studies, convergence, benchmark, warm-up."""
