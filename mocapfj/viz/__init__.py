"""mocapfj.viz"""
