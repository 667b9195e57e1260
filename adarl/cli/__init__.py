"""Command-line interface: `adarl <command>`; each command lives in its own module here."""
