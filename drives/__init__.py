"""Fieldbus masters behind one Drive interface, and the CiA-402 protocol tables."""
