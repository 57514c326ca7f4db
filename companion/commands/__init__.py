"""Subcommands of ``companion``; each module defines ``register(subparsers)``."""
