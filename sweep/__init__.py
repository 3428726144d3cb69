"""sweep package (work in progress)."""
