"""Where maps come from: point masses, spherical harmonics, random fields, FFT
continuation, EGM2008 regional builds (and, with the ``mag`` extra, magnetic maps)."""

from jaxgrav.fields import harmonics, pointmass, random, spectral

__all__ = ["harmonics", "pointmass", "random", "spectral"]
