"""Subcommands of ``springbench`` (see harness.cli.COMMANDS)."""
