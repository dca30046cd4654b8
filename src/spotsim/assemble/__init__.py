"""Scenario -> Model: the scene described by its XACRO, its contact faces and sphere layers, and the compiled Model."""
