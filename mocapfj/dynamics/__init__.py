"""mocapfj.dynamics"""
