/* The map made from the world (loaded by twin/nav/map_server/_native.py): the flood fill that
   finds the region the robot stands in. */

#include <math.h>
#include <stdlib.h>

/* The 4-connected region of cells not `blocked` holding cell `start` (row-major index): region[i] = 1.
   Returns the region's size, or -1 when memory runs out. */
long twin_flood_fill(const unsigned char *blocked, long rows, long cols, long start, unsigned char *region) {
    long n = rows * cols, size = 0, top = 0;
    for (long i = 0; i < n; ++i) region[i] = 0;
    if (start < 0 || start >= n || blocked[start]) return 0;
    long *stack = malloc(sizeof(long) * (size_t)n);
    if (!stack) return -1;
    region[start] = 1;
    stack[top++] = start;
    while (top > 0) {
        long c = stack[--top];
        size++;
        long r = c / cols, k = c % cols;
        long next[4] = {r > 0 ? c - cols : -1, r < rows - 1 ? c + cols : -1,
                        k > 0 ? c - 1 : -1, k < cols - 1 ? c + 1 : -1};
        for (int j = 0; j < 4; ++j) {
            long m = next[j];
            if (m >= 0 && !blocked[m] && !region[m]) {
                region[m] = 1;
                stack[top++] = m;
            }
        }
    }
    free(stack);
    return size;
}
