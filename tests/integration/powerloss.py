"""A simulated power loss over a directory tree, from the log faultfs.c keeps in power-loss mode
(FAULTFS_LOG): what survives is what was fsynced, the pessimistic model of LevelDB's
FaultInjectionTestEnv.
  - A name survives only if its directory was fsynced while the name was in it (the directory's
    last sync decides: a name it no longer lists is gone, a name added since is lost).
  - A file's content is its content at its last fsync; a file never synced is empty.
  - The root itself (which the test made before the run) survives; a directory never synced keeps
    no entries.
Inodes tie the records together, so renames need no records of their own."""
import os
import shutil


def read_log(log):
    """{inode: [(inode, is_dir, name)]} of each directory's last sync, {inode: blob} of each file's."""
    directories, files = {}, {}
    with open(log) as f:
        lines = f.read().split("\n")
    i = 0
    while i < len(lines):
        parts = lines[i].split(" ", 2)
        if parts[0] == "F":
            files[int(parts[1])] = parts[2]
            i += 1
        elif parts[0] == "D":
            count = int(parts[2])
            entries = []
            for line in lines[i + 1:i + 1 + count]:
                inode, kind, name = line.split(" ", 2)
                entries.append((int(inode), kind == "d", name))
            directories[int(parts[1])] = entries
            i += 1 + count
        else:
            i += 1
    return directories, files


def power_loss(root, log):
    """Replaces root by the tree a power loss would leave (the tree before it goes to root + '.lost').
    Returns (names lost, files whose content was cut) relative to the tree before."""
    directories, files = read_log(log) if os.path.exists(log) else ({}, {})
    blobs = log + ".blobs"
    root_inode = os.stat(root).st_ino
    before = set()
    for d, subdirs, names in os.walk(root):
        for n in subdirs + names:
            before.add(os.path.relpath(os.path.join(d, n), root))
    lost = root + ".lost"
    os.rename(root, lost)
    os.makedirs(root)
    after, cut = set(), 0

    def rebuild(inode, path):
        nonlocal cut
        for child, is_dir, name in directories.get(inode, []):
            target = os.path.join(path, name)
            after.add(os.path.relpath(target, root))
            if is_dir:
                os.makedirs(target)
                rebuild(child, target)
            elif child in files:
                shutil.copyfile(os.path.join(blobs, files[child]), target)
                volatile = os.path.join(lost, os.path.relpath(target, root))
                if os.path.exists(volatile) and os.path.getsize(volatile) != os.path.getsize(target):
                    cut += 1
            else:
                open(target, "wb").close()
                cut += 1

    rebuild(root_inode, root)
    return sorted(before - after), cut
