"""The passivity analysis of the sampled-data wall loop: plant, responses, criterion, limits.

Pure numerics (numpy, scipy): nothing here imports bus code.  SI units throughout.
"""
