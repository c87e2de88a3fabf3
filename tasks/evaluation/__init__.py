"""Stage package ``evaluation`` of the refine data flow (see DEVELOPERS.md)."""
