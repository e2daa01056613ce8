"""Built-in scenarios (TOML files)."""
