"""monitor package (work in progress)."""
