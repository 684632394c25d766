"""handle_drake: learning dexterous grasping and in-hand manipulation on Drake."""

__version__ = "0.1.0"
