"""From words to sub-task samples: state split and encodings."""
