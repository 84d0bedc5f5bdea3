"""Differential-testing oracle: random BT.CPP v4 trees run through behaviortreepy."""
