"""orchestrator package (work in progress)."""
