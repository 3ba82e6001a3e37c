"""hardware_mocks"""
