#!/bin/sh
# Add winder to the desktop menu of the current user (run from the unpacked dist/winder folder):
#
#   ./install-desktop-entry.sh            install ~/.local/share/applications/winder.desktop + icons
#   ./install-desktop-entry.sh --remove   take them away again
#
# The entry starts this folder's `winder` by its absolute path, so move the folder first, then run this.
set -eu

here=$(cd "$(dirname "$0")" && pwd)
data=${XDG_DATA_HOME:-$HOME/.local/share}
apps="$data/applications"
icons="$data/icons/hicolor"

if [ "${1:-}" = "--remove" ]; then
    rm -f "$apps/winder.desktop" "$icons/scalable/apps/winder.svg" "$icons/256x256/apps/winder.png"
    echo "removed the winder desktop entry"
else
    mkdir -p "$apps" "$icons/scalable/apps" "$icons/256x256/apps"
    cp "$here/_internal/resources/icons/winder.svg" "$icons/scalable/apps/winder.svg"
    cp "$here/_internal/resources/icons/winder.png" "$icons/256x256/apps/winder.png"
    sed -e "s|^Exec=.*|Exec=\"$here/winder\" %f|" -e "s|^TryExec=.*|TryExec=$here/winder|" \
        "$here/winder.desktop" > "$apps/winder.desktop"
    chmod 644 "$apps/winder.desktop"
    echo "installed $apps/winder.desktop (starts $here/winder)"
fi
command -v update-desktop-database >/dev/null 2>&1 && update-desktop-database -q "$apps" || true
command -v gtk-update-icon-cache >/dev/null 2>&1 && gtk-update-icon-cache -q -t "$icons" || true
