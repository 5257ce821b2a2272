"""Score stage: each camera pose's localizability from its points and the tags it sees."""
