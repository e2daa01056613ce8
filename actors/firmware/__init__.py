"""actors/firmware"""
