// What happens on the page, for the modules that react to it: each event
// has a fixed name, listeners run in the order they were added (each
// module's setup, called in order by viewer.js), and an unknown name throws.

const LISTENERS = {
  opened: [], // (opened): a stream's `opened` message arrived
  received: [], // (frame): a stream frame arrived (every one; keep it cheap: nothing drawn)
  frame: [], // (frame): the newest frame is shown (once per animation frame at most), after its pose is applied
  pose: [], // (pose): a pose applied (a frame's or a paused view's); may move state.positions
  overlay: [], // (ctx, cam, dpr): the scene is drawn; draw over it
  listChanged: [], // (): the clip list or the clip selected changed: show it again
  clipSelected: [], // (clip): a clip was selected
  clipAdopted: [], // (clip): a crossfade made its clip the page's
  characterChanged: [], // (character | null, adopted): the motion plays on another character (character.js)
  jointSelected: [], // (name | null): a joint was picked in the view
  refused: [], // (problem): the server refused a control
  redraw: [], // (): the scene needs drawing again
};

function listeners(name) {
  const list = LISTENERS[name];
  if (!list) throw new Error(`no page event "${name}"`);
  return list;
}

export function on(name, listener) {
  listeners(name).push(listener);
}

export function emit(name, ...args) {
  for (const listener of listeners(name)) listener(...args);
}
