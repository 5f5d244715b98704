"""ASTCom: discover, read, write, call and stream every variable of a device controller."""
