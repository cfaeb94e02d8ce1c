// Where the page keeps what outlives a reload: the IndexedDB database "quilting", its object
// store "history" (one record per result, by an increasing id), behind a few promises. A
// browser without IndexedDB (some private windows) gets a store in memory with the same
// methods instead, which lasts as long as the page.

/** The database, its version and its one object store. */
const DATABASE = "quilting";
const VERSION = 1;
const HISTORY = "history";

/** A promise of an IDBRequest's result (its error rejects). */
function answer(request) {
  return new Promise((resolve, reject) => {
    request.onsuccess = () => resolve(request.result);
    request.onerror = () => reject(request.error);
  });
}

/** A promise that the transaction ``tx`` has committed (its error, or abort, rejects). */
function committed(tx) {
  return new Promise((resolve, reject) => {
    tx.oncomplete = () => resolve();
    tx.onerror = () => reject(tx.error);
    tx.onabort = () => reject(tx.error || new Error("the transaction was aborted"));
  });
}

/** The records of ``store`` in ``database``: added (oldest dropped past a cap), listed,
 * removed one by one or all at once. Every method is a promise. */
class DatabaseStore {
  constructor(database) {
    this.database = database;
    this.persistent = true;
  }

  /** ``mode`` transaction on the history store: [transaction, store]. */
  open(mode) {
    const tx = this.database.transaction(HISTORY, mode);
    return [tx, tx.objectStore(HISTORY)];
  }

  /** Every record, newest first. */
  async all() {
    const [, store] = this.open("readonly");
    return (await answer(store.getAll())).reverse();
  }

  /** Add ``record`` and drop the oldest past ``keep`` records, in one transaction; its id. */
  async add(record, keep) {
    const [tx, store] = this.open("readwrite");
    let id = null;
    store.add(record).onsuccess = (event) => {
      id = event.target.result;
    };
    store.getAllKeys().onsuccess = (event) => {
      const keys = event.target.result; // ascending: the oldest first
      for (const old of keys.slice(0, Math.max(0, keys.length - keep))) store.delete(old);
    };
    await committed(tx);
    return id;
  }

  async remove(id) {
    const [tx, store] = this.open("readwrite");
    store.delete(id);
    await committed(tx);
  }

  async clear() {
    const [tx, store] = this.open("readwrite");
    store.clear();
    await committed(tx);
  }
}

/** The history store's methods over a list in memory, where there is no IndexedDB: nothing
 * is kept past the page. */
export class MemoryStore {
  constructor() {
    this.records = []; // oldest first
    this.next = 1;
    this.persistent = false;
  }

  async all() {
    return [...this.records].reverse();
  }

  async add(record, keep) {
    const id = this.next;
    this.next += 1;
    this.records.push({ ...record, id });
    this.records.splice(0, Math.max(0, this.records.length - keep));
    return id;
  }

  async remove(id) {
    this.records = this.records.filter((record) => record.id !== id);
  }

  async clear() {
    this.records = [];
  }
}

/**
 * The history store of IndexedDB (database "quilting", store "history", records keyed by an
 * auto-incremented ``id``). Rejects when this browser has no IndexedDB or refuses to open it.
 */
export async function openHistoryStore() {
  let request;
  try {
    request = window.indexedDB.open(DATABASE, VERSION);
  } catch (error) { // no indexedDB at all, or one that throws (some private windows)
    throw new Error(`IndexedDB is not available here (${error.message})`);
  }
  request.onupgradeneeded = () => {
    request.result.createObjectStore(HISTORY, { keyPath: "id", autoIncrement: true });
  };
  const database = await answer(request);
  // Another tab upgrading the database: let it, this page's store then stops answering.
  database.onversionchange = () => database.close();
  return new DatabaseStore(database);
}
