"""Applications: each experiment and its command; the only layer that knows more
than one device or task."""
