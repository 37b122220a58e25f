"""Restorers: one attacker per file, each rebuilding the sharp scene from sensor images
(``attacks.base.Restorer``). Fixed filters (identity, raw, gray-world, demosaic-vng), known-PSF
deconvolution (wiener-known-psf, richardson-lucy-known-psf) and trained networks (nafnet-generic,
nafnet-known-pairs, training-adversary)."""
