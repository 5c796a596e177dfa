"""mocapfj.discover"""
