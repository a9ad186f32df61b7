"""The `linkevo` subcommands, one module each."""
