"""One module per ``canest`` sub-command; each has ``register(subparsers)``."""
