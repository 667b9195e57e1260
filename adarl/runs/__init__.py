"""The run-folder format (docs/run-format.md): layout, lock, logs, checkpoints, provenance."""
