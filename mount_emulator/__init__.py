"""A 10 kHz two-axis direct-drive alt-azimuth mount behind an ASTCom Endpoint."""
