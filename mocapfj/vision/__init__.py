"""mocapfj.vision"""
