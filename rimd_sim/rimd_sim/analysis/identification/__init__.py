"""analysis/identification"""
