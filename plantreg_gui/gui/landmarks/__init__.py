"""The landmark page: click point pairs, fit / nudge / refine the rig, see the overlay (issue 8)."""
