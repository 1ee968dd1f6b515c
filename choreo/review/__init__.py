"""Reading run logs back: summary, frames, timeline, export, replay."""
