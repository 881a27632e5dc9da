"""User-facing tools: the crackgen CLI, gallery, show and benchmarks."""
