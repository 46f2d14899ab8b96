"""Builders of the visibility skeleton, one module per level (docs/skeleton.md).

Builders are functions of in-memory data (a Scene, lower levels) returning flat
arrays; they never touch files.
"""
