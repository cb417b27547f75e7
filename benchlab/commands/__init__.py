"""One module per `benchlab` command (see benchlab.cli)."""
