// Errors of the JS ASTCom client.
//
//   AstcomError                 every error of this module; `.code` is the wire code or 0
//   ├── ProtocolError           the endpoint sent something the spec does not allow
//   ├── ConnectionClosed        the connection is gone (or never opened)
//   ├── AuthenticationFailed    401, or the endpoint's proof did not match the password
//   └── RemoteError             an ERR reply to a request (400..503); `.op` names the request

export class AstcomError extends Error {
  constructor(message, code = 0) {
    super(message);
    this.name = this.constructor.name;
    this.code = code;
  }
}

export class ProtocolError extends AstcomError {}

export class ConnectionClosed extends AstcomError {}

export class AuthenticationFailed extends AstcomError {}

export class RemoteError extends AstcomError {
  constructor(op, code, message) {
    super(`${op}: ERR ${code}: ${message}`, code);
    this.op = op;
    this.remoteMessage = message;
  }
}
