"""analysis/dynamics"""
