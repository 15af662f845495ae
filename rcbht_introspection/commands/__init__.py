"""CLI subcommands: thin argument parsing over the core modules."""
