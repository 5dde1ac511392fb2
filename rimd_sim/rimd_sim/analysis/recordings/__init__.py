"""analysis/recordings"""
