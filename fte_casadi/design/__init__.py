"""Design: augmented system, H and assumption checks, LMIs, certificates, the Design record."""

from .record import Design as Design
