"""Robot models shipped with pinobs (installed as ``pinobs._models``); see README.md."""
