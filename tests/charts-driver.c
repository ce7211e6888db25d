/*
 * charts-driver DIR: draws the charts of the bench run in DIR with
 * tw_charts_write(), for test-charts.sh. Exit 0, or 1 with one line on
 * stderr.
 */
#include <stdio.h>

#include "tools/tileworld/charts.h"

int main(int argc, char **argv)
{
    if (argc != 2) {
        fprintf(stderr, "charts-driver: usage: charts-driver DIR\n");
        return 2;
    }
    char err[2048];
    if (tw_charts_write(argv[1], err, sizeof(err)) != 0) {
        fprintf(stderr, "charts-driver: %s\n", err);
        return 1;
    }
    return 0;
}
