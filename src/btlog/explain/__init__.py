"""Explanations of behavior-tree executions."""
