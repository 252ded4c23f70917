"""Data packaged with the firmware: the normative ankle-angle curve used as the gait reference."""
