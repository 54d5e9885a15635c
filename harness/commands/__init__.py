"""Subcommands of ``springbench`` (see harness.registry.COMMANDS)."""
