"""Place stage: k tags chosen among the candidates by a named placement method."""
