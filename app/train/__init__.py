"""Training of Headway's learned models (`headway train ...`)."""
