"""Interfaces stage: command line and Python API."""
