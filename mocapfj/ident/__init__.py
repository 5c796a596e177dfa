"""mocapfj.ident"""
