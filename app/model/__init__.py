"""The physics: material law, incremental potential, loading, and the discrete problem."""
