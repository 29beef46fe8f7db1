// Reconnection delays: exponential from BASE_MS to MAX_MS with +-JITTER, so that the viewers
// of a restarted server do not all come back in the same millisecond.
export const BASE_MS = 500;
export const MAX_MS = 8000;
export const JITTER = 0.2;

export class Backoff {
  private attempts = 0;

  constructor(private readonly random: () => number = Math.random) {}

  /** The delay before the next attempt; each call doubles the next one, up to MAX_MS. */
  next(): number {
    const nominal = Math.min(MAX_MS, BASE_MS * 2 ** this.attempts);
    this.attempts = Math.min(this.attempts + 1, 30);
    return Math.round(nominal * (1 + JITTER * (2 * this.random() - 1)));
  }

  get attemptCount(): number {
    return this.attempts;
  }

  /** A stream worked again: start from BASE_MS next time. */
  reset(): void {
    this.attempts = 0;
  }
}
