"""The demo experiments shipped with the plugin (Builder files and their conditions)."""
