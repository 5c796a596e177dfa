"""mocapfj.joints"""
