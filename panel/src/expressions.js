// Algebraic expressions over streamed signals, parsed by mathjs (never eval).
//
// Dotted signal names (`axis.az.error`, `gains[1]`) would read as property accesses in
// mathjs, so each name that is a known column is replaced by a plain identifier first.
import { create, all } from 'mathjs';

const math = create(all);
// Expressions are typed by users: keep mathjs from redefining its own functions.
const parse = math.parse;
math.import({
  import: () => { throw new Error('import is disabled'); },
  createUnit: () => { throw new Error('createUnit is disabled'); },
  evaluate: () => { throw new Error('evaluate is disabled'); },
  parse: () => { throw new Error('parse is disabled'); },
  simplify: () => { throw new Error('simplify is disabled'); },
  derivative: () => { throw new Error('derivative is disabled'); },
}, { override: true });

const NAME_RE = /[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*(?:\[\d+\])*/g;

/**
 * Compile `text` over the columns `names`; return {evaluate(row) -> number, uses: [names]}.
 * `row` maps column name -> value. Throws Error with mathjs's message on a syntax error
 * or when the expression names something that is neither a column nor a math function.
 */
export function compileExpression(text, names, extraScope = {}) {
  const known = new Set(names);
  const uses = [];
  const source = text.replace(NAME_RE, (token) => {
    if (!known.has(token)) return token;
    let i = uses.indexOf(token);
    if (i < 0) i = uses.push(token) - 1;
    return `__s${i}`;
  });
  const node = parse(source);
  const compiled = node.compile();
  const scope = new Map(Object.entries(extraScope));
  // Every free symbol must be a column, an extra variable or a mathjs constant/function.
  node.traverse((n) => {
    if (n.type === 'SymbolNode' && !n.name.startsWith('__s') && !scope.has(n.name) && !(n.name in math)) {
      throw new Error(`unknown name ${n.name}: not a streamed signal (${names.length ? names.join(', ') : 'none streaming'})`);
    }
    if (n.type === 'AssignmentNode' || n.type === 'FunctionAssignmentNode') {
      throw new Error('assignments are not allowed in an expression');
    }
  });
  return {
    uses,
    evaluate(row) {
      for (let i = 0; i < uses.length; i++) scope.set(`__s${i}`, row[uses[i]]);
      const v = compiled.evaluate(scope);
      return typeof v === 'number' ? v : Number(v);
    },
    evaluateWith(vars) {
      for (const [k, v] of Object.entries(vars)) scope.set(k, v);
      const v = compiled.evaluate(scope);
      return typeof v === 'number' ? v : Number(v);
    },
  };
}
