"""The `cpgsim` command line: entry point (`main`), graph catalog, shared helpers, one module per command."""
