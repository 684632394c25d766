"""The base layer: hands, models, checks, paths and the small shared helpers.

Imports nothing else of handle_drake."""
