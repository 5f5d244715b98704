// Units a plot axis may be shown in: angles (and their rates and accelerations) in radians,
// degrees or arcseconds, whatever unit the endpoint's LIST gives. Other units are shown as
// they come. The samples and the CSV export keep the endpoint's unit.

const ANGLE = { rad: 1, deg: 180 / Math.PI, arcsec: (180 / Math.PI) * 3600 };
const ANGLE_NAMES = { rad: 'rad', deg: 'deg', '°': 'deg', degree: 'deg', degrees: 'deg', arcsec: 'arcsec', '″': 'arcsec', '"': 'arcsec' };

/** Split a unit into its angle part and the rest: 'rad/s' -> ['rad', '/s']; null if no angle. */
function angleUnit(unit) {
  const m = /^\s*(rad|deg|°|degrees?|arcsec|″|")(\s*\/.*)?$/.exec(unit || '');
  return m ? [ANGLE_NAMES[m[1]], (m[2] || '').trim()] : null;
}

/** Return the units `unit` may be shown in (itself first), e.g. 'rad/s' -> ['rad/s', 'deg/s', 'arcsec/s']. */
export function unitChoices(unit) {
  const a = angleUnit(unit);
  if (!a) return [unit || ''];
  const [base, rest] = a;
  return [`${base}${rest}`, ...Object.keys(ANGLE).filter((k) => k !== base).map((k) => `${k}${rest}`)];
}

/** Return the factor from `unit` to `shown` (1 when they are the same or not convertible). */
export function unitFactor(unit, shown) {
  const a = angleUnit(unit);
  const b = angleUnit(shown);
  if (!a || !b || a[1] !== b[1]) return 1;
  return ANGLE[b[0]] / ANGLE[a[0]];
}
