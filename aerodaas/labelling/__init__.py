"""From footage to labels: frames worth labelling, pre-labels, and the Label Studio round trip."""
