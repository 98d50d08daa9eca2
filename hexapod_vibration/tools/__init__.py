"""Command-line tools: the experiment runner, analyze, shared process control."""
