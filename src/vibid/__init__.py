"""vibid: stepped-sine vibration tests of thin plates and identification of their stiffness."""

__version__ = "0.1.0"
