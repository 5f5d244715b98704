"""The `vs` command line: thin Typer commands over the virtualstar library."""
