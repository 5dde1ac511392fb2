"""ros/clients"""
